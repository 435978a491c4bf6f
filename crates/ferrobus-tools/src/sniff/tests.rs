use std::time::Duration;

use ferrobus_proto::crc::crc16;
use ferrobus_proto::frame::{LineConfig, LineTiming};
use ferrobus_proto::sniff::{FragmentKind, Role};
use tokio::sync::mpsc;

use super::capture::packet;
use super::reader::{Chunk, Stamped};
use super::*;
use crate::pcapng::Content;

fn timing() -> LineTiming {
    LineTiming::new(&LineConfig::new(9600).unwrap())
}

/// `body` with its CRC.
fn adu(body: &[u8]) -> Vec<u8> {
    let mut frame = body.to_vec();
    frame.extend_from_slice(&crc16(body).to_le_bytes());
    frame
}

/// Read 2 holding registers of unit 1 from 0.
fn request() -> Vec<u8> {
    adu(&[0x01, 0x03, 0x00, 0x00, 0x00, 0x02])
}

/// Its reply: 1 and 2.
fn reply() -> Vec<u8> {
    adu(&[0x01, 0x03, 0x04, 0x00, 0x01, 0x00, 0x02])
}

/// A listener fed by the returned sender, as the reading thread would feed it.
fn listener() -> (mpsc::UnboundedSender<Chunk>, Listener) {
    let (tx, rx) = mpsc::unbounded_channel();
    (tx, Listener::over(Box::new(Stamped::new(rx)), timing(), "/dev/test".into(), 0))
}

fn now() -> tokio::time::Instant {
    tokio::time::Instant::now()
}

#[tokio::test(start_paused = true)]
async fn a_request_and_its_reply_are_paired_with_the_response_time_on_the_shared_clock() {
    let (tx, mut listener) = listener();
    let start = now();
    tx.send(Chunk::Bytes(request(), now())).unwrap();
    tokio::time::advance(Duration::from_millis(30)).await;
    tx.send(Chunk::Bytes(reply(), now())).unwrap();
    let first = listener.next().await.unwrap().unwrap();
    let second = listener.next().await.unwrap().unwrap();
    let BusEvent::Frame { role: Role::Request, crc_ok: true, time: asked, .. } = first else { panic!("{first:?}") };
    let BusEvent::Frame { role: Role::Response, crc_ok: true, time: answered, response_time, bytes } = second else {
        panic!("{second:?}")
    };
    assert_eq!(bytes, reply());
    assert_eq!(response_time, Some(Duration::from_millis(30)));
    // Instants count from the Unix epoch: the request's end is the clock's epoch, stamped.
    assert_eq!(asked.end, listener.clock.unix(start));
    assert!(asked.end.as_nanos() >= listener.clock.unix_at_epoch);
    assert_eq!(answered.end.saturating_duration_since(asked.end), Duration::from_millis(30));
}

#[tokio::test(start_paused = true)]
async fn a_frame_cut_short_comes_out_when_the_sleeper_reaches_the_decoders_deadline() {
    let (tx, mut listener) = listener();
    let cut = request().get(..4).unwrap().to_vec();
    tx.send(Chunk::Bytes(cut.clone(), now())).unwrap();
    let sent = now();
    // Nothing more comes: the paused clock runs to the decoder's deadline, and no further.
    let event = listener.next().await.unwrap().unwrap();
    let BusEvent::Fragment { bytes, kind: FragmentKind::Partial { expected: Some(8) }, time } = event else {
        panic!("{event:?}")
    };
    assert_eq!(bytes, cut);
    let waited = now().duration_since(sent);
    assert!(waited >= timing().t1_5(), "woken after {waited:?}");
    assert!(waited <= PC_INCOMPLETE_TIMEOUT + Duration::from_millis(1), "woken after {waited:?}");
    assert_eq!(time.end, listener.clock.unix(sent));
}

#[tokio::test(start_paused = true)]
async fn a_read_error_comes_after_the_events_before_it_and_ends_the_listener() {
    let (tx, mut listener) = listener();
    tx.send(Chunk::Bytes(request(), now())).unwrap();
    tx.send(Chunk::Failed(io::Error::from_raw_os_error(5))).unwrap();
    assert!(matches!(listener.next().await, Ok(Some(BusEvent::Frame { role: Role::Request, .. }))));
    let error = listener.next().await.unwrap_err();
    assert!(matches!(&error, SniffError::Read { path, .. } if path == "/dev/test"), "{error:?}");
    assert!(error.to_string().starts_with("reading /dev/test: "), "{error}");
    assert_eq!(error.io_error().raw_os_error(), Some(5));
    assert!(matches!(Error::from(error), Error::Io { .. }));
    assert!(matches!(listener.next().await, Ok(None)));
}

#[tokio::test(start_paused = true)]
async fn the_end_of_the_port_ends_the_listener_and_finish_settles_what_it_held() {
    let (tx, mut listener) = listener();
    tx.send(Chunk::Bytes(vec![0x01, 0x03], now())).unwrap();
    drop(tx);
    // The port ended before the decoder's deadline: the two bytes are still held.
    assert!(matches!(listener.next().await, Ok(None)));
    let (held, failure) = listener.finish();
    assert!(
        matches!(held.as_slice(), [BusEvent::Fragment { bytes, kind: FragmentKind::Partial { .. }, .. }] if bytes == &[1, 3]),
        "{held:?}"
    );
    assert!(failure.is_none());
    assert!(listener.finish().0.is_empty());
}

#[tokio::test(start_paused = true)]
async fn finish_hears_what_the_reading_thread_had_read_and_a_read_error_after_it() {
    let (tx, mut listener) = listener();
    // Read before listening stopped, never asked for by `next`: a request and its reply.
    tx.send(Chunk::Bytes(request(), now())).unwrap();
    tokio::time::advance(Duration::from_millis(30)).await;
    tx.send(Chunk::Bytes(reply(), now())).unwrap();
    tx.send(Chunk::Failed(io::Error::other("unplugged"))).unwrap();
    let (heard, failure) = listener.finish();
    let roles: Vec<Role> = heard
        .iter()
        .map(|e| match e {
            BusEvent::Frame { role, crc_ok: true, .. } => *role,
            other => panic!("{other:?}"),
        })
        .collect();
    assert_eq!(roles, [Role::Request, Role::Response], "{heard:?}");
    assert!(matches!(&failure, Some(SniffError::Read { path, .. }) if path == "/dev/test"), "{failure:?}");
    let (nothing, none) = listener.finish();
    assert!(nothing.is_empty() && none.is_none());
}

#[tokio::test(start_paused = true)]
async fn each_chunk_is_stamped_with_its_arrival_not_with_when_the_caller_came_to_take_it() {
    let (tx, mut listener) = listener();
    let asked = now();
    tx.send(Chunk::Bytes(request(), asked)).unwrap();
    tokio::time::advance(Duration::from_millis(30)).await;
    let answered = now();
    tx.send(Chunk::Bytes(reply(), answered)).unwrap();
    // The caller comes back a second later: both chunks wait, with their stamps.
    tokio::time::advance(Duration::from_secs(1)).await;
    let Some(BusEvent::Frame { time: first, .. }) = listener.next().await.unwrap() else { panic!("no request") };
    let Some(BusEvent::Frame { time: second, response_time, .. }) = listener.next().await.unwrap() else {
        panic!("no reply")
    };
    assert_eq!((first.end, second.end), (listener.clock.unix(asked), listener.clock.unix(answered)));
    assert_eq!(response_time, Some(Duration::from_millis(30)));
}

#[test]
fn the_port_the_pump_is_handed_refuses_every_write() {
    let (_tx, rx) = mpsc::unbounded_channel();
    let mut port: BoxPort = Box::new(Stamped::new(rx));
    let runtime = tokio::runtime::Builder::new_current_thread().build().unwrap();
    let written = runtime.block_on(tokio::io::AsyncWriteExt::write_all(&mut port, &request()));
    assert_eq!(written.unwrap_err().kind(), io::ErrorKind::PermissionDenied);
}

#[cfg(unix)]
#[tokio::test]
async fn a_listener_on_a_pty_holds_it_alone_hears_a_frame_stamped_as_it_came_and_writes_nothing_back() {
    use ferrobus::port::{Port, Pty};
    use ferrobus_proto::frame::Parity;
    use tokio::io::AsyncWriteExt;

    let mut pty = Pty::open().unwrap();
    let line = LineConfig::new(9600).unwrap().with_parity(Parity::None);
    let mut listener = Listener::open(SerialConfig::new(&pty.path, line), timing()).unwrap();
    // Held exclusively: a second listener is refused while the first listens.
    let second = Listener::open(SerialConfig::new(&pty.path, line), timing()).unwrap_err();
    assert_eq!(second.io_error().kind(), io::ErrorKind::ResourceBusy, "{second}");
    let before = listener.clock.unix(now());
    pty.port.write_all(&request()).await.unwrap();
    let heard = tokio::time::timeout(Duration::from_secs(5), listener.next()).await.unwrap().unwrap();
    let after = listener.clock.unix(now());
    let Some(BusEvent::Frame { role: Role::Request, crc_ok: true, bytes, time, .. }) = heard else {
        panic!("{heard:?}")
    };
    assert_eq!(bytes, request());
    assert!(before <= time.end && time.end <= after, "stamped {:?} outside the read", time.end);
    tokio::time::sleep(Duration::from_millis(20)).await;
    let mut back = [0u8; 64];
    assert_eq!(pty.port.read_buffered(&mut back).unwrap(), 0, "the listener wrote to the port");
    assert!(listener.finish().0.is_empty());
    // Finished, the port is let go at once (its thread ends without waiting for a chunk).
    let mut again = Listener::open(SerialConfig::new(&pty.path, line), timing());
    for _ in 0..100 {
        if again.is_ok() {
            break;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
        again = Listener::open(SerialConfig::new(&pty.path, line), timing());
    }
    assert!(again.is_ok(), "the finished listener still holds the port: {:?}", again.err());
}

#[test]
fn an_open_error_names_the_port_and_its_settings_and_keeps_the_os_error() {
    let line = LineConfig::new(9600).unwrap();
    let serial = SerialConfig::new("/nonexistent/ferrobus-sniff-test", line);
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    let error = runtime.block_on(async { Listener::open(serial, timing()) }).unwrap_err();
    assert!(matches!(&error, SniffError::Open { path, .. } if path == "/nonexistent/ferrobus-sniff-test"));
    assert!(error.to_string().starts_with(&format!("opening /nonexistent/ferrobus-sniff-test at {line}: ")), "{error}");
    assert_eq!(error.io_error().kind(), io::ErrorKind::NotFound);
}

fn frame(role: Role, bytes: Vec<u8>, crc_ok: bool, response_time: Option<Duration>) -> BusEvent {
    let time = WireTime {
        start: Instant::from_nanos(0),
        end: Instant::from_nanos(1),
        silence_before: None,
        longest_gap: Duration::ZERO,
        t3_5_violation: false,
        t1_5_violation: false,
    };
    BusEvent::Frame { bytes, role, crc_ok, time, response_time }
}

fn noise(len: usize) -> BusEvent {
    let BusEvent::Frame { time, .. } = frame(Role::Request, request(), true, None) else { unreachable!() };
    BusEvent::Fragment { bytes: vec![0xFF; len], kind: FragmentKind::Noise, time }
}

#[test]
fn the_filter_takes_units_and_function_codes_an_exception_as_its_function_and_noise_only_unfiltered() {
    let exception = frame(Role::Response, adu(&[0x02, 0x83, 0x02]), true, None);
    let unanswered = BusEvent::Unanswered { unit: 3, function: 0x10, request_end: Instant::from_nanos(0) };
    let everything = Filter::default();
    assert!(everything.admits(&exception) && everything.admits(&unanswered) && everything.admits(&noise(2)));
    let reads = Filter { units: vec![], functions: vec![0x03] };
    assert!(reads.admits(&exception));
    assert!(!reads.admits(&unanswered));
    assert!(!reads.admits(&noise(2)));
    let unit_3 = Filter { units: vec![3], functions: vec![] };
    assert!(!unit_3.admits(&exception));
    assert!(unit_3.admits(&unanswered));
}

#[test]
fn stats_count_per_unit_requests_responses_exceptions_crc_errors_and_the_bytes_outside_frames() {
    let mut stats = Stats::default();
    stats.count(&frame(Role::Request, request(), true, None));
    stats.count(&frame(Role::Response, reply(), true, Some(Duration::from_millis(10))));
    stats.count(&frame(Role::Response, adu(&[0x01, 0x83, 0x02]), false, Some(Duration::from_millis(30))));
    stats.count(&BusEvent::Unanswered { unit: 1, function: 3, request_end: Instant::from_nanos(0) });
    stats.count(&noise(3));
    let unit = stats.units.get(&1).unwrap();
    assert_eq!((unit.requests, unit.responses, unit.exceptions), (1, 2, 1));
    assert_eq!((unit.unanswered, unit.crc_errors), (1, 1));
    let (min, mean, max) = unit.response_spread().unwrap();
    assert_eq!((min, mean, max), (Duration::from_millis(10), Duration::from_millis(20), Duration::from_millis(30)));
    assert_eq!((stats.noise_runs, stats.partial_frames, stats.noise_bytes), (1, 0, 3));
    assert_eq!(UnitStats::default().response_spread(), None);
}

#[test]
fn a_packet_says_what_was_wrong_with_a_frame_in_its_comment_and_an_unanswered_request_is_no_packet() {
    let mut bad = request();
    if let Some(last) = bad.last_mut() {
        *last ^= 0xFF;
    }
    let event = frame(Role::Request, bad, false, None);
    let (p, comment) = packet(&event, timing().char_time()).unwrap();
    assert_eq!(p.content, Content::Request);
    assert_eq!(p.timestamp_ns, 1);
    let should = crc16(&[0x01, 0x03, 0x00, 0x00, 0x00, 0x02]);
    assert!(comment.unwrap().contains(&format!("should be 0x{should:04x}")));
    let noise = noise(2);
    let (p, comment) = packet(&noise, timing().char_time()).unwrap();
    assert_eq!((p.content, comment.as_deref()), (Content::Other, Some("noise: 2 bytes that start no frame")));
    let unanswered = BusEvent::Unanswered { unit: 1, function: 3, request_end: Instant::from_nanos(0) };
    assert!(packet(&unanswered, timing().char_time()).is_none());
}

#[test]
fn a_capture_writes_a_packet_per_frame_after_its_headers() {
    let writer = crate::pcapng::PcapngWriter::new(Vec::new(), "tty", "RS-485").unwrap();
    let headers = writer.into_inner().len();
    let writer = crate::pcapng::PcapngWriter::new(Vec::new(), "tty", "RS-485").unwrap();
    let mut capture = SniffCapture::new(writer, &timing());
    capture.write(&frame(Role::Request, request(), true, None)).unwrap();
    capture.write(&BusEvent::Unanswered { unit: 1, function: 3, request_end: Instant::from_nanos(0) }).unwrap();
    capture.flush().unwrap();
    let out = capture.into_inner().into_inner();
    assert!(out.len() > headers);
    let frame = request();
    assert!(out.windows(frame.len()).any(|w| w == frame.as_slice()), "the frame's bytes are in the capture");
}

#[test]
fn a_listener_and_its_next_event_may_move_between_threads() {
    fn send<T: Send>(_: &T) {}
    let (_tx, mut listener) = listener();
    send(&listener);
    send(&listener.next());
}
