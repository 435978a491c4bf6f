//! The endpoint over real HTTP on loopback: each path, its type, and a source that fails.

use std::sync::Mutex;

use tokio::io::{AsyncReadExt, AsyncWriteExt};

use super::*;

/// A source with one counter and a health that a test sets.
#[derive(Debug)]
struct Fake {
    requests: u64,
    failing: Mutex<Option<String>>,
}

impl Collector for Fake {
    fn encode(&self, mut encoder: DescriptorEncoder<'_>) -> Result<(), std::fmt::Error> {
        let mut out = Family::on(&mut encoder);
        out.counter("fake_requests", "Requests.", [(Labels::of(&[("line", "0")]).with("unit", 7), self.requests)])?;
        let mut h = hdrhistogram::Histogram::<u64>::new(2).unwrap();
        h.record(3_000).unwrap();
        h.record(40_000).unwrap();
        out.seconds_histogram("fake_response", "Response time.", &RESPONSE_BOUNDS, [(Labels::none(), &h)])
    }
}

impl Source for Fake {
    fn status(&self) -> Status {
        let mut table = Table::new("Units", &["unit", "name"]);
        table.rows.push(vec!["7".into(), "<b>pump</b>".into()]);
        Status { service: "fake".into(), summary: "one unit".into(), tables: vec![table] }
    }
    fn health(&self) -> Health {
        self.failing.lock().unwrap().clone().map_or(Health::Ok, Health::Failing)
    }
}

/// GET `path`: the status line, the headers and the body.
async fn get(addr: std::net::SocketAddr, path: &str) -> (String, String, String) {
    let mut stream = tokio::net::TcpStream::connect(addr).await.unwrap();
    let request = format!("GET {path} HTTP/1.1\r\nHost: test\r\nConnection: close\r\n\r\n");
    stream.write_all(request.as_bytes()).await.unwrap();
    let mut answer = String::new();
    stream.read_to_string(&mut answer).await.unwrap();
    let (head, body) = answer.split_once("\r\n\r\n").unwrap();
    let (status, headers) = head.split_once("\r\n").unwrap();
    (status.to_string(), headers.to_ascii_lowercase(), body.to_string())
}

async fn start(source: Arc<Fake>) -> std::net::SocketAddr {
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    tokio::spawn(serve(listener, source));
    addr
}

#[tokio::test]
async fn metrics_are_openmetrics_with_counters_histograms_and_the_eof() {
    let addr = start(Arc::new(Fake { requests: 42, failing: Mutex::new(None) })).await;
    let (status, headers, body) = get(addr, "/metrics").await;
    assert_eq!(status, "HTTP/1.1 200 OK");
    assert!(headers.contains("content-type: application/openmetrics-text; version=1.0.0"), "{headers}");
    assert!(body.contains("# TYPE ferrobus_fake_requests counter\n"), "{body}");
    assert!(body.contains("ferrobus_fake_requests_total{line=\"0\",unit=\"7\"} 42\n"), "{body}");
    assert!(body.contains("# TYPE ferrobus_fake_response_seconds histogram\n"), "{body}");
    assert!(body.contains("ferrobus_fake_response_seconds_bucket{le=\"0.005\"} 1\n"), "3 ms is below 5 ms: {body}");
    assert!(body.contains("ferrobus_fake_response_seconds_bucket{le=\"0.05\"} 2\n"), "{body}");
    assert!(body.contains("ferrobus_fake_response_seconds_bucket{le=\"+Inf\"} 2\n"), "{body}");
    assert!(body.contains("ferrobus_fake_response_seconds_count 2\n"), "{body}");
    assert!(body.ends_with("# EOF\n"), "{body}");
}

#[tokio::test]
async fn healthz_is_200_while_healthy_and_503_with_why_when_not() {
    let source = Arc::new(Fake { requests: 0, failing: Mutex::new(None) });
    let addr = start(Arc::clone(&source)).await;
    assert_eq!(get(addr, "/healthz").await.2, "ok\n");
    *source.failing.lock().unwrap() = Some("no unit answered".into());
    let (status, _, body) = get(addr, "/healthz").await;
    assert_eq!((status.as_str(), body.as_str()), ("HTTP/1.1 503 Service Unavailable", "failing: no unit answered\n"));
}

#[tokio::test]
async fn the_page_and_its_data_are_served_and_no_text_is_html() {
    let addr = start(Arc::new(Fake { requests: 1, failing: Mutex::new(None) })).await;
    let (status, headers, page) = get(addr, "/").await;
    assert_eq!(status, "HTTP/1.1 200 OK");
    assert!(headers.contains("content-type: text/html"), "{headers}");
    assert!(page.contains("status.json") && !page.contains("innerHTML"), "the page sets text only");
    let (_, headers, body) = get(addr, "/status.json").await;
    assert!(headers.contains("cache-control: no-store"), "{headers}");
    let status: Value = serde_json::from_str(&body).unwrap();
    assert_eq!(status["service"], "fake");
    assert_eq!(status["health"]["ok"], true);
    assert_eq!(status["tables"][0]["rows"][0][1], "<b>pump</b>", "a value is passed as it is, for textContent");
    assert!(status["recent"].is_array());
    let (status, _, _) = get(addr, "/nothing").await;
    assert_eq!(status, "HTTP/1.1 404 Not Found");
}

#[test]
fn the_recent_warnings_keep_the_last_twenty_newest_first() {
    let recent = Recent::new();
    for i in 0..25 {
        recent.push(format!("warning {i}"));
    }
    let list = recent.list();
    assert_eq!(list.len(), Recent::KEEP);
    assert_eq!((list[0]["text"].as_str(), list[19]["text"].as_str()), (Some("warning 24"), Some("warning 5")));
}
