//! The checker itself, before it checks the bridge: a small edge session built with
//! pysparkplug and published through mosquitto passes `verify.py`; the same session with one
//! rule broken (a skipped seq, no DBIRTH, an NDEATH with another bdSeq, an unknown alias, an
//! NBIRTH with seq 1) fails it with that rule named. A session that ends without DISCONNECT
//! gets its Will NDEATH from the broker, QoS 1, with the NBIRTH's bdSeq. pysparkplug's own
//! EdgeNode (0.6.1) is caught breaking two rules. And the broker harness: stopped and started
//! again on its port, it keeps a recorder's session and what was published meanwhile.

use super::spb::{self, Recorder};
use crate::support::mosquitto::Broker;

/// Records one `publish.py session ARGS` and verifies the recording.
fn recorded_session(name: &str, args: &[&str]) -> spb::Verdict {
    let broker = Broker::start();
    let dir = spb::evidence_dir(name);
    let recorder = Recorder::start(&broker, &dir, &[]);
    let mut session = vec!["session", "--group", "g", "--node", "n", "--device", "d", "--data", "6"];
    session.extend_from_slice(args);
    spb::publish(&broker, &session);
    recorder
        .wait_until("the session's NDEATH", std::time::Duration::from_secs(10), |m| spb::count(m, "NDEATH", None) == 1);
    let path = recorder.stop();
    spb::verify(&path, &["--expect-unit", "d/speed=Hz", "--series", "d/speed"])
}

#[test]
fn a_session_that_follows_the_rules_passes_and_its_will_carries_the_nbirth_bdseq() {
    let Some(_turn) = spb::require() else { return };
    for (name, args) in [("checker-clean", &[][..]), ("checker-killed", &["--kill"][..])] {
        let verdict = recorded_session(name, args);
        verdict.assert_clean();
        let sessions = verdict.sessions();
        assert_eq!(sessions.len(), 1, "{verdict}");
        let session = &sessions[0];
        assert_eq!(session["bdseq"], 7, "{verdict}");
        assert_eq!(session["ndeath_bdseq"], 7, "{verdict}");
        assert_eq!(session["ndeath_qos"], 1, "the NDEATH (a Will when killed) is QoS 1: {verdict}");
        assert_eq!(session["messages"], 8, "NBIRTH, DBIRTH, 6 DDATA: {verdict}");
        assert_eq!(verdict.metric("d", "speed", "unit"), "Hz", "{verdict}");
        let values: Vec<f64> = verdict.series("d", "speed").iter().filter_map(|p| p["value"].as_f64()).collect();
        assert_eq!(values, [0.0, 1.0, 2.0, 3.0, 4.0, 5.0], "{verdict}");
    }
}

#[test]
fn each_broken_rule_is_caught_and_named() {
    let Some(_turn) = spb::require() else { return };
    for (spoil, expected) in [
        ("seq", "DDATA g/n/d: seq 6, expected 5"),
        ("birth", "DDATA g/n/d: no DBIRTH of the device before it in this session"),
        ("bdseq", "NDEATH g/n: bdSeq 8 differs from the session's NBIRTH bdSeq 7"),
        ("alias", "DDATA g/n/d: alias 99 is not in the device's DBIRTH"),
        ("nbirth-seq", "NBIRTH g/n: seq 1, the spec wants 0"),
    ] {
        let verdict = recorded_session(&format!("checker-{spoil}"), &["--break", spoil]);
        assert_eq!(verdict.code, 1, "--break {spoil}: verify.py must fail\n{verdict}");
        assert!(
            verdict.errors().iter().any(|e| e.ends_with(expected)),
            "--break {spoil}: no error ending {expected:?}\n{verdict}"
        );
    }
}

#[test]
fn a_recording_that_is_not_sparkplug_fails_the_check() {
    let Some(_turn) = spb::require() else { return };
    let dir = spb::evidence_dir("checker-garbage");
    let path = dir.join("recording.jsonl");
    let lines = [
        // DDATA before any NBIRTH, with a payload that is not protobuf at all.
        r#"{"topic": "spBv1.0/g/DDATA/n/d", "qos": 0, "retain": false, "payload": "ffffffff", "received": 0}"#,
        r#"{"topic": "spBv1.0/g/NBIRTH/n/extra", "qos": 0, "retain": false, "payload": "", "received": 0}"#,
        "not json",
    ];
    std::fs::write(&path, lines.join("\n")).expect("writing the recording");
    let verdict = spb::verify(&path, &[]);
    assert_eq!(verdict.code, 1, "{verdict}");
    let errors = verdict.errors();
    assert!(errors.iter().any(|e| e.contains("does not decode as a Sparkplug B Payload")), "{verdict}");
    assert!(errors.iter().any(|e| e.contains("NBIRTH takes no device id")), "{verdict}");
    assert!(errors.iter().any(|e| e.contains("not a JSON line")), "{verdict}");
}

#[test]
fn a_broker_started_again_on_its_port_keeps_a_recorders_session_and_what_came_meanwhile() {
    let Some(_turn) = spb::require() else { return };
    let mut broker = Broker::start_persistent();
    let dir = spb::evidence_dir("checker-broker-restart");
    let recorder = Recorder::start(&broker, &dir, &["t/#"]);
    spb::publish(&broker, &["text", "--topic", "t/before", "--payload", "1"]);
    broker.stop();
    broker.start_again();
    // At once, before the recorder is back: the restored session queues it.
    spb::publish(&broker, &["text", "--topic", "t/after", "--payload", "2", "--qos", "0"]);
    let messages = recorder.wait_until("t/before and t/after", std::time::Duration::from_secs(10), |m| {
        m.iter().any(|m| m.topic == "t/after")
    });
    std::thread::sleep(std::time::Duration::from_millis(300));
    let topics: Vec<String> = recorder.messages().iter().map(|m| format!("{}={}", m.topic, m.text())).collect();
    assert_eq!(topics, ["t/before=1", "t/after=2"], "{}\nbroker log:\n{}", spb::listing(&messages), broker.log());
}

#[test]
fn pysparkplugs_own_edge_node_is_caught_sending_an_ndeath_with_the_next_bdseq() {
    let Some(_turn) = spb::require() else { return };
    let broker = Broker::start();
    let dir = spb::evidence_dir("checker-pysparkplug-edge-node");
    let recorder = Recorder::start(&broker, &dir, &[]);
    spb::publish(&broker, &["edge-node", "--group", "g", "--node", "n", "--device", "d"]);
    recorder.wait_until("its NDEATH", std::time::Duration::from_secs(10), |m| spb::count(m, "NDEATH", None) == 1);
    let verdict = spb::verify(&recorder.stop(), &[]);
    // pysparkplug 0.6.1's EdgeNode prepares the Will again after the NBIRTH, so the NDEATH of
    // its clean disconnect carries the next connection's bdSeq.
    let errors = verdict.errors();
    assert!(
        errors.iter().any(|e| e.ends_with("NDEATH g/n: bdSeq 1 differs from the session's NBIRTH bdSeq 0")),
        "{verdict}"
    );
    assert!(errors.iter().any(|e| e.contains("no Boolean metric 'Node Control/Rebirth'")), "{verdict}");
}
