//! Pairing to named values on explicit frames: each test hands [`Pairing::take`] the events a
//! listener would, with their wire times.

use std::time::{Duration, UNIX_EPOCH};

use ferrobus_profile::{NOT_IMPLEMENTED, Profile, Value};
use ferrobus_proto::Instant;
use ferrobus_proto::crc::crc16;
use ferrobus_proto::sniff::{Role, WireTime};

use super::*;

/// Unit 1: `speed` (u16 at 0, ×0.01 Hz), `total` (u32 at 1-2, low word first), `state` (u16
/// at 3, an enumeration, 0xFFFF not implemented), `cmd` (u16 at 4, write-only); coil `run` at 0.
const PROFILE: &str = "[device]\nname='toy'\nvendor='v'\nproduct_code='p'\nrevision='1'\n\
     [[registers]]\nnumber=0\nname='speed'\nscale=0.01\nunit='Hz'\n\
     [[registers]]\nnumber=1\nname='total'\ntype='u32'\norder='CDAB'\n\
     [[registers]]\nnumber=3\nname='state'\nvalues={ '0' = 'stopped', '1' = 'running' }\nnot_implemented=0xFFFF\n\
     [[registers]]\nnumber=4\nname='cmd'\naccess='wo'\n\
     [[coils]]\nnumber=0\nname='run'\n";

fn profile() -> Profile {
    Profile::parse(PROFILE, "toy.toml").expect("the toy profile")
}

/// `body` with its CRC.
fn adu(body: &[u8]) -> Vec<u8> {
    let mut frame = body.to_vec();
    frame.extend_from_slice(&crc16(body).to_le_bytes());
    frame
}

fn at(ms: u64) -> WireTime {
    WireTime::at(Instant::from_nanos(1_700_000_000_000_000_000 + ms * 1_000_000))
}

fn request(body: &[u8], ms: u64) -> BusEvent {
    BusEvent::Frame { bytes: adu(body), role: Role::Request, crc_ok: true, time: at(ms), response_time: None }
}

/// A reply at `ms`, paired (as the core pairs it) with a request that ended at `asked`.
fn reply(body: &[u8], asked: u64, ms: u64) -> BusEvent {
    BusEvent::Frame {
        bytes: adu(body),
        role: Role::Response,
        crc_ok: true,
        time: at(ms),
        response_time: Some(Duration::from_millis(ms - asked)),
    }
}

/// What `events` give, in order.
fn heard(events: &[BusEvent]) -> Vec<Heard> {
    let mut pairing = Pairing::new();
    events.iter().filter_map(|e| pairing.take(e)).collect()
}

/// `(code, shown, scaled)` of what one heard reply says of the profile's points.
fn shown(heard: &Heard) -> Vec<(String, String, Option<f64>)> {
    let Some(group) = heard.group(&profile()) else { return Vec::new() };
    let sample = heard.sample(0, 0, &group).expect("the group's own sample");
    let readings = sample.result.expect("readings");
    readings.iter().map(|r| (group.cells[r.cell].name.clone(), r.shown.clone(), r.scaled)).collect()
}

#[test]
fn a_read_reply_gives_every_point_it_holds_decoded_as_a_poll_decodes_it_at_the_replys_time() {
    // Holding 0..4: speed 5000 (50.00 Hz), total 0x0001_0002 low word first, state 1.
    let got = heard(&[
        request(&[0x01, 0x03, 0x00, 0x00, 0x00, 0x04], 10),
        reply(&[0x01, 0x03, 0x08, 0x13, 0x88, 0x00, 0x02, 0x00, 0x01, 0x00, 0x01], 10, 25),
    ]);
    let [one] = got.as_slice() else { panic!("{got:?}") };
    assert_eq!((one.unit, one.table, one.start, one.written), (1, Table::Holding, 0, false));
    assert_eq!(one.time, UNIX_EPOCH + Duration::from_millis(1_700_000_000_025));
    assert_eq!(one.response_time, Duration::from_millis(15));
    assert_eq!(
        shown(one),
        [
            ("speed".to_string(), "50.00 Hz".to_string(), Some(50.0)),
            ("total".to_string(), "65538".to_string(), Some(65538.0)),
            ("state".to_string(), "running".to_string(), Some(1.0)),
        ]
    );
    let group = one.group(&profile()).unwrap();
    assert_eq!(group.name, "u1 speed..state");
    assert_eq!(one.traffic.tx, [0x01, 0x03, 0x00, 0x00, 0x00, 0x04]);
}

#[test]
fn a_point_the_reply_holds_only_part_of_is_left_out() {
    // Holding 2..4: the second word of total, state, and cmd (write-only: not read).
    let got = heard(&[
        request(&[0x01, 0x03, 0x00, 0x02, 0x00, 0x03], 0),
        reply(&[0x01, 0x03, 0x06, 0x00, 0x07, 0x00, 0x00, 0x00, 0x09], 0, 5),
    ]);
    let [one] = got.as_slice() else { panic!("{got:?}") };
    assert_eq!(shown(one), [("state".to_string(), "stopped".to_string(), Some(0.0))]);
    // Holding 1 alone: half of total, nothing whole.
    let half =
        heard(&[request(&[0x01, 0x03, 0x00, 0x01, 0x00, 0x01], 0), reply(&[0x01, 0x03, 0x02, 0x00, 0x07], 0, 5)]);
    assert_eq!(half.len(), 1);
    assert_eq!(half[0].group(&profile()), None);
}

#[test]
fn the_word_order_is_the_points_so_low_word_first_reads_the_first_register_as_the_low_word() {
    let got = heard(&[
        request(&[0x01, 0x03, 0x00, 0x01, 0x00, 0x02], 0),
        reply(&[0x01, 0x03, 0x04, 0x56, 0x78, 0x12, 0x34], 0, 5),
    ]);
    let [one] = got.as_slice() else { panic!("{got:?}") };
    let group = one.group(&profile()).unwrap();
    let sample = one.sample(0, 0, &group).unwrap();
    let readings = sample.result.unwrap();
    assert_eq!(readings[0].raw, Ok(Value::Int(0x1234_5678)));
}

#[test]
fn an_exception_a_bad_crc_and_a_reply_of_another_function_give_nothing() {
    let ask = || request(&[0x01, 0x03, 0x00, 0x00, 0x00, 0x01], 0);
    assert_eq!(heard(&[ask(), reply(&[0x01, 0x83, 0x02], 0, 5)]), []);
    let mut bad = reply(&[0x01, 0x03, 0x02, 0x00, 0x07], 0, 5);
    if let BusEvent::Frame { crc_ok, .. } = &mut bad {
        *crc_ok = false;
    }
    assert_eq!(heard(&[ask(), bad]), []);
    assert_eq!(heard(&[ask(), reply(&[0x01, 0x04, 0x02, 0x00, 0x07], 0, 5)]), []);
    // A count that is not the request's.
    assert_eq!(heard(&[ask(), reply(&[0x01, 0x03, 0x04, 0x00, 0x07, 0x00, 0x08], 0, 5)]), []);
}

#[test]
fn an_unanswered_request_gives_nothing_and_a_later_reply_pairs_with_nothing() {
    let unanswered = BusEvent::Unanswered { unit: 1, function: 3, request_end: at(0).end };
    let stray = reply(&[0x01, 0x03, 0x02, 0x00, 0x07], 0, 5);
    assert_eq!(heard(&[request(&[0x01, 0x03, 0x00, 0x00, 0x00, 0x01], 0), unanswered, stray.clone()]), []);
    // A reply whose response time is not from the request kept: not that request's.
    assert_eq!(heard(&[request(&[0x01, 0x03, 0x00, 0x00, 0x00, 0x01], 1), stray]), []);
    // And a reply the core paired with nothing.
    let unpaired = BusEvent::Frame {
        bytes: adu(&[0x01, 0x03, 0x02, 0x00, 0x07]),
        role: Role::Response,
        crc_ok: true,
        time: at(5),
        response_time: None,
    };
    assert_eq!(heard(&[request(&[0x01, 0x03, 0x00, 0x00, 0x00, 0x01], 0), unpaired]), []);
}

#[test]
fn a_not_implemented_value_is_shown_as_not_implemented_never_as_a_reading() {
    let got = heard(&[request(&[0x01, 0x03, 0x00, 0x03, 0x00, 0x01], 0), reply(&[0x01, 0x03, 0x02, 0xFF, 0xFF], 0, 5)]);
    let [one] = got.as_slice() else { panic!("{got:?}") };
    assert_eq!(shown(one), [("state".to_string(), NOT_IMPLEMENTED.to_string(), None)]);
    let group = one.group(&profile()).unwrap();
    let readings = one.sample(0, 0, &group).unwrap().result.unwrap();
    let point = &group.cells[0].point;
    assert!(!point.implemented(readings[0].raw.as_ref().unwrap()));
    assert_eq!(point.number(readings[0].raw.as_ref().unwrap()), "", "CSV's value is empty");
}

#[test]
fn an_acknowledged_write_gives_the_values_written_and_an_unacknowledged_one_nothing() {
    // 0x06: cmd (write-only, so only a write shows it) = 7, echoed.
    let single =
        heard(&[request(&[0x01, 0x06, 0x00, 0x04, 0x00, 0x07], 0), reply(&[0x01, 0x06, 0x00, 0x04, 0x00, 0x07], 0, 5)]);
    let [one] = single.as_slice() else { panic!("{single:?}") };
    assert!(one.written);
    assert_eq!(shown(one), [("cmd".to_string(), "7".to_string(), Some(7.0))]);
    // 0x10: speed and total, acknowledged with their start and count.
    let multiple = heard(&[
        request(&[0x01, 0x10, 0x00, 0x00, 0x00, 0x03, 0x06, 0x11, 0x94, 0x00, 0x01, 0x00, 0x00], 0),
        reply(&[0x01, 0x10, 0x00, 0x00, 0x00, 0x03], 0, 5),
    ]);
    let [one] = multiple.as_slice() else { panic!("{multiple:?}") };
    assert_eq!(
        shown(one),
        [("speed".to_string(), "45.00 Hz".to_string(), Some(45.0)), ("total".to_string(), "1".to_string(), Some(1.0))]
    );
    // 0x05: the run coil on.
    let coil =
        heard(&[request(&[0x01, 0x05, 0x00, 0x00, 0xFF, 0x00], 0), reply(&[0x01, 0x05, 0x00, 0x00, 0xFF, 0x00], 0, 5)]);
    let [one] = coil.as_slice() else { panic!("{coil:?}") };
    assert_eq!((one.table, one.items.as_slice()), (Table::Coils, [1].as_slice()));
    assert_eq!(shown(one), [("run".to_string(), "1".to_string(), Some(1.0))]);
    // Refused with an exception, or never answered: nothing was written.
    assert_eq!(heard(&[request(&[0x01, 0x06, 0x00, 0x04, 0x00, 0x07], 0), reply(&[0x01, 0x86, 0x03], 0, 5)]), []);
    let unanswered = BusEvent::Unanswered { unit: 1, function: 6, request_end: at(0).end };
    assert_eq!(heard(&[request(&[0x01, 0x06, 0x00, 0x04, 0x00, 0x07], 0), unanswered]), []);
}

#[test]
fn a_group_of_its_own_gets_the_readings_of_the_cells_the_reply_holds_with_their_indices() {
    // A poller's group of speed..state (as a bridge's device has it): a reply of holding 3
    // alone gives the reading of its third cell only.
    let groups = Group::points(&profile(), 1, &["speed".into(), "total".into(), "state".into()], &[], Duration::ZERO)
        .expect("one group");
    let [group] = groups.as_slice() else { panic!("{groups:?}") };
    let got = heard(&[request(&[0x01, 0x03, 0x00, 0x03, 0x00, 0x01], 0), reply(&[0x01, 0x03, 0x02, 0x00, 0x01], 0, 5)]);
    let sample = got[0].sample(4, 9, group).expect("state is in the group");
    assert_eq!((sample.group, sample.seq), (4, 9));
    let readings = sample.result.unwrap();
    assert_eq!(readings.iter().map(|r| (r.cell, r.shown.as_str())).collect::<Vec<_>>(), [(2, "running")]);
    let other_unit = Group { unit: 2, ..group.clone() };
    assert_eq!(got[0].sample(0, 0, &other_unit), None);
}
