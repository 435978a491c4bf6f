//! Fault rules aimed at requests, through the simulator's own seams: `Sim::admit` for the
//! actions taken when a request arrives, `FaultFilter` for those taken on its reply, byte
//! for byte.

use std::time::Duration;

use ferrobus::Framing;
use ferrobus::server::{Answering, Fate, ReplyFilter, Shared};
use ferrobus_proto::frame::rtu::{self, RtuFrame};
use ferrobus_proto::frame::{AduHeader, mbap};
use ferrobus_proto::pdu::{AddressRange, Request};
use ferrobus_proto::slave::{Admission, Handler};
use ferrobus_proto::{ExceptionCode, FunctionCode};
use ferrobus_sim::{Device, FaultFilter, Faults, Profile, Sim, tokio_clock};

/// A generic device at unit 1 with the fault specifications `specs`, merged in order.
fn sim(specs: &[&str]) -> Shared<Sim> {
    let mut faults = Faults::default();
    for spec in specs {
        faults.merge(spec.parse().unwrap_or_else(|e| panic!("{spec}: {e}")));
    }
    let mut sim = Sim::new(tokio_clock(), 1);
    sim.add(1, Device::new(Profile::load("generic").unwrap()), faults);
    Shared::new(sim)
}

/// A read of `quantity` holding registers from `start`, as the server reports it.
fn read_holding(start: u16, quantity: u16) -> Answering {
    Answering {
        unit: 1,
        function: FunctionCode::ReadHoldingRegisters,
        addresses: [AddressRange::from_quantity(start, quantity), None],
    }
}

/// The reply to a read of two registers, 0x1234 and 0x5678: 03 04 12 34 56 78.
const PDU: [u8; 6] = [0x03, 0x04, 0x12, 0x34, 0x56, 0x78];

fn rtu_reply(unit: u8, pdu: &[u8]) -> Vec<u8> {
    let mut out = [0u8; rtu::MAX_ADU_LEN];
    let n = rtu::encode_pdu(unit, pdu, &mut out).unwrap();
    out[..n].to_vec()
}

fn tcp_reply(transaction: u16, pdu: &[u8]) -> Vec<u8> {
    let mut out = [0u8; mbap::MAX_ADU_LEN];
    let n = mbap::encode_pdu(AduHeader { unit: 1, transaction }, pdu, &mut out).unwrap();
    out[..n].to_vec()
}

/// What the filter makes of the RTU reply to `answering`.
fn filtered(sim: &Shared<Sim>, framing: Framing, answering: &Answering, frame: &[u8]) -> (Fate, Vec<u8>) {
    let mut filter = FaultFilter::new(sim.clone(), framing);
    let mut frame = frame.to_vec();
    let fate = filter.filter(Some(answering), &mut frame);
    (fate, frame)
}

#[test]
fn an_exception_rule_refuses_only_its_function_and_addresses() {
    let sim = sim(&["fc=3,addr=0x10-0x1F,exception=0x06"]);
    let mut handler = sim.clone();
    let admit = |h: &mut Shared<Sim>, pdu: &[u8]| h.lock().admit(1, false, &Request::parse(pdu).unwrap());
    // 03 000F 0002 touches 0x10.
    assert_eq!(
        admit(&mut handler, &[0x03, 0x00, 0x0F, 0x00, 0x02]),
        Admission::Refuse(ExceptionCode::ServerDeviceBusy)
    );
    assert_eq!(admit(&mut handler, &[0x03, 0x00, 0x20, 0x00, 0x02]), Admission::Serve);
    assert_eq!(admit(&mut handler, &[0x04, 0x00, 0x10, 0x00, 0x01]), Admission::Serve);
    // A broadcast is never answered: no rule refuses it.
    assert_eq!(
        handler.lock().admit(1, true, &Request::parse(&[0x06, 0x00, 0x10, 0x00, 0x01]).unwrap()),
        Admission::Serve
    );
}

#[test]
fn a_no_reply_rule_ignores_the_request() {
    let sim = sim(&["fc=6,addr=7,no-reply"]);
    let handler = sim.clone();
    assert_eq!(
        handler.lock().admit(1, false, &Request::parse(&[0x06, 0x00, 0x07, 0x00, 0x01]).unwrap()),
        Admission::Ignore
    );
    assert_eq!(
        handler.lock().admit(1, false, &Request::parse(&[0x06, 0x00, 0x08, 0x00, 0x01]).unwrap()),
        Admission::Serve
    );
}

#[test]
fn a_short_rule_sends_the_first_half_or_the_first_n_bytes() {
    let reply = rtu_reply(1, &PDU);
    let half = sim(&["fc=3,short"]);
    assert_eq!(filtered(&half, Framing::Rtu, &read_holding(0, 2), &reply), (Fate::Send, reply[..4].to_vec()));
    let three = sim(&["fc=3,short=3"]);
    assert_eq!(filtered(&three, Framing::Rtu, &read_holding(0, 2), &reply), (Fate::Send, reply[..3].to_vec()));
}

#[test]
fn a_malformed_reply_is_one_pdu_byte_short_under_a_valid_checksum() {
    let sim = sim(&["malformed"]);
    let (fate, frame) = filtered(&sim, Framing::Rtu, &read_holding(0, 2), &rtu_reply(1, &PDU));
    assert_eq!(fate, Fate::Send);
    assert_eq!(frame, rtu_reply(1, &PDU[..5]));
    let checked = RtuFrame::new_checked(&frame).expect("a valid CRC");
    assert_eq!(checked.pdu(), [0x03, 0x04, 0x12, 0x34, 0x56]);
    // Modbus/TCP: the MBAP length follows the shorter PDU.
    let (_, frame) = filtered(&sim, Framing::Mbap, &read_holding(0, 2), &tcp_reply(9, &PDU));
    assert_eq!(frame, [0x00, 0x09, 0x00, 0x00, 0x00, 0x06, 0x01, 0x03, 0x04, 0x12, 0x34, 0x56]);
}

#[test]
fn a_unit_rule_sends_the_reply_from_another_unit_with_its_checksum() {
    let sim = sim(&["addr=0-1,unit=7"]);
    assert_eq!(filtered(&sim, Framing::Rtu, &read_holding(0, 2), &rtu_reply(1, &PDU)).1, rtu_reply(7, &PDU));
    // Outside the range, untouched.
    assert_eq!(filtered(&sim, Framing::Rtu, &read_holding(2, 2), &rtu_reply(1, &PDU)).1, rtu_reply(1, &PDU));
}

#[test]
fn a_transaction_rule_changes_the_mbap_id_and_leaves_serial_replies_alone() {
    let plus = sim(&["tid=+1"]);
    assert_eq!(filtered(&plus, Framing::Mbap, &read_holding(0, 2), &tcp_reply(0xFFFF, &PDU)).1, tcp_reply(0, &PDU));
    let fixed = sim(&["tid=0x1234"]);
    assert_eq!(filtered(&fixed, Framing::Mbap, &read_holding(0, 2), &tcp_reply(5, &PDU)).1, tcp_reply(0x1234, &PDU));
    assert_eq!(filtered(&fixed, Framing::Rtu, &read_holding(0, 2), &rtu_reply(1, &PDU)).1, rtu_reply(1, &PDU));
}

#[test]
fn delay_and_trickle_rules_set_the_fate_and_keep_the_bytes() {
    let reply = rtu_reply(1, &PDU);
    let delay = sim(&["fc=3,delay=250ms"]);
    assert_eq!(
        filtered(&delay, Framing::Rtu, &read_holding(0, 2), &reply),
        (Fate::Delay(Duration::from_millis(250)), reply.clone())
    );
    let trickle = sim(&["fc=3,trickle=5ms"]);
    assert_eq!(
        filtered(&trickle, Framing::Rtu, &read_holding(0, 2), &reply),
        (Fate::Trickle { gap: Duration::from_millis(5) }, reply.clone())
    );
    // Another function code: sent as it is.
    let coils = Answering { function: FunctionCode::ReadCoils, ..read_holding(0, 2) };
    assert_eq!(filtered(&trickle, Framing::Rtu, &coils, &reply), (Fate::Send, reply));
}

#[test]
fn the_first_matching_rule_applies_and_a_zero_share_never_does() {
    let reply = rtu_reply(1, &PDU);
    let sim = sim(&["fc=3,share=0%,short", "fc=3,delay=10ms", "fc=3,trickle=1ms"]);
    for _ in 0..20 {
        assert_eq!(filtered(&sim, Framing::Rtu, &read_holding(0, 2), &reply).0, Fate::Delay(Duration::from_millis(10)));
    }
}

#[test]
fn a_reply_without_a_known_request_meets_only_the_unit_wide_faults() {
    let sim = sim(&["fc=3,short"]);
    let mut filter = FaultFilter::new(sim, Framing::Rtu);
    let mut frame = rtu_reply(1, &PDU);
    assert_eq!(filter.filter(None, &mut frame), Fate::Send);
    assert_eq!(frame, rtu_reply(1, &PDU));
}

#[test]
fn a_unit_answered_by_another_units_device_meets_that_devices_rules() {
    let sim = sim(&["fc=3,exception=0x06", "fc=4,trickle=1ms"]);
    sim.lock().alias(0xFF, 1);
    let handler = sim.clone();
    let read = Request::parse(&[0x03, 0x00, 0x00, 0x00, 0x01]).unwrap();
    assert_eq!(handler.lock().admit(0xFF, false, &read), Admission::Refuse(ExceptionCode::ServerDeviceBusy));
    let input = Answering { unit: 0xFF, function: FunctionCode::ReadInputRegisters, ..read_holding(0, 1) };
    let (fate, _) = filtered(&sim, Framing::Mbap, &input, &tcp_reply(1, &[0x04, 0x02, 0x00, 0x01]));
    assert_eq!(fate, Fate::Trickle { gap: Duration::from_millis(1) });
}
